"""The ``probe`` module (probe.json) on the real runtime: ``echo`` answers at once, ``work`` after a delay."""
from modules.runtime import BasicModule


class Probe(BasicModule):
    concurrent = True

    def echo(self, tag):
        return {"tag": tag}

    def work(self, seconds, tag):
        self.context.sleep(seconds.data)
        return {"tag": tag}
