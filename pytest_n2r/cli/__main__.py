"""``python -m pytest_n2r.cli``: the ``n2r`` command where its script is not on ``PATH`` (a ``pip install --user``
whose scripts folder is not, a notebook's kernel)."""

import sys

from .main import main

sys.exit(main())
