"""``python -m sixdpose``: same as the ``sixdpose`` console script."""

import sys

from sixdpose.cli import main

sys.exit(main())
