import sys

from bsdfkit.cli import main

sys.exit(main())
