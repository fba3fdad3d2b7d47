import sys

from negstiff.cli import main

sys.exit(main())
