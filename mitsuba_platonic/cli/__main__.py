"""``python -m mitsuba_platonic.cli`` (as torchrun launches training): the ``platonic`` command."""

from ..console import main

main()
