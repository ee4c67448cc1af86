"""The README's example module: a gripper that opens 10 cm at most."""
from modules import BasicModule, Failure


class Gripper(BasicModule):
    def open(self, width):
        if width.data > 0.1:
            raise Failure("the gripper opens 10 cm at most")
        self.context.sleep(0.05)
        return {"success": True}

    def close(self):
        return {"success": True, "holding": True}
