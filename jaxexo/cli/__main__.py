"""``python -m jaxexo.cli``: the ``jaxexo`` command."""

import sys

from jaxexo.cli import main

sys.exit(main())
