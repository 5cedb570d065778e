"""`python -m hrgjax.cli`: the `hrgjax` command."""

import sys

from . import main

sys.exit(main())
