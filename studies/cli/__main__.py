import sys

from studies.cli.parser import main

if __name__ == "__main__":  # not when a spawned worker process imports the main module
    sys.exit(main())
