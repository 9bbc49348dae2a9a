"""``python -m abb_gym``: the ``abb-gym`` command line (:mod:`abb_gym.cli`)."""
import sys

from .cli import main

sys.exit(main())
