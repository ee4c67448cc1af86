"""``python -m coordinator`` is the ``bmtree`` command."""
import sys

from coordinator.cli import main

sys.exit(main())
