"""Module ``m<N>`` with functions ``f0``..``f<K-1>`` (``many_<N>.json``, written by the load test),
each echoing its tag: the load test runs dozens of these."""
import sys

from modules.definition import load_definition
from modules.node import run_module
from modules.runtime import BasicModule


def _echo(self, tag):
    return {"tag": tag}


definition = load_definition(sys.argv[1])
cls = type("Many", (BasicModule,), dict({name: _echo for name in definition.functions}, concurrent=True))
sys.exit(run_module(definition, cls(), "bm_%s" % definition.name))
