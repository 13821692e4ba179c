import sys

from mjx_pusht.cli import main

sys.exit(main())
