"""python -m gmis: the gmis command line."""

import sys

from gmis.cli import main

sys.exit(main())
