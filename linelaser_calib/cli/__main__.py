"""``python -m linelaser_calib.cli``: the command line."""

from __future__ import annotations

import sys

from linelaser_calib.cli.parser import main

sys.exit(main())
