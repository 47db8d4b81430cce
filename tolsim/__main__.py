import sys

from tolsim.cli import main

sys.exit(main())
