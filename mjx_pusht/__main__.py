import sys

from mjx_pusht.cli.commands import main

sys.exit(main())
