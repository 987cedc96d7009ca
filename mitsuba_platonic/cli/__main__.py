"""``python -m mitsuba_platonic.cli`` (as torchrun launches training): the ``platonic`` command."""

import sys

from . import main

sys.exit(main())
