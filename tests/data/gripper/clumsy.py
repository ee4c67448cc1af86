"""A gripper whose open() has a bug: its traceback must reach the module's terminal and /rosout."""
from modules import BasicModule


class Gripper(BasicModule):
    def open(self, width):
        return {"success": width.data / 0.0 > 1}

    def close(self):
        return {"success": True, "holding": True}
