import sys

from . import main

# guarded, so that importing the module (the API reference does) does not run the command line
if __name__ == "__main__":
    sys.exit(main())
