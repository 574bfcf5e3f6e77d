"""``python -m scattertrack``: the same as the ``scattertrack`` command."""

import sys

from scattertrack.cli import main

sys.exit(main())
