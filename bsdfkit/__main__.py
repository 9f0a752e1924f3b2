import sys

from bsdfkit.cli.main import main

sys.exit(main())
