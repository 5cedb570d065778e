"""`python -m hrgjax.cli`: the `hrgjax` command."""

import sys

from . import main

if __name__ == "__main__":  # importing the module (pkgutil.walk_packages, docs tools) runs nothing
    sys.exit(main())
