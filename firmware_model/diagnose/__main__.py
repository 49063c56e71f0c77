"""``python -m firmware_model.diagnose``: see :mod:`firmware_model.diagnose.cli`."""

import sys

from .cli import main

sys.exit(main())
