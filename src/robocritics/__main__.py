"""``python -m robocritics``: the same command line as ``robocritics``."""

import sys

from robocritics.cli.main import main

sys.exit(main())
