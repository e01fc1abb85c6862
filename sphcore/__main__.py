import sys

from sphcore.cli import main

sys.exit(main())
