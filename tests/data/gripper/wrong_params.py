from modules import BasicModule


class Gripper(BasicModule):
    def open(self, size):
        return {"success": True}

    def close(self):
        return {"success": True, "holding": True}
