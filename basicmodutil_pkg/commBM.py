"""``from basicmodutil_pkg import commBM`` keeps working: it is :mod:`comm.commBM`."""
from comm.commBM import *  # noqa: F401,F403
from comm.commBM import __all__  # noqa: F401
