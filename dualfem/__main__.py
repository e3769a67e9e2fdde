import sys

from dualfem.cli.main import main

sys.exit(main())
