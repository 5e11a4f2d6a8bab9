import sys

from motorid.cli import main

sys.exit(main())
