"""``python -m toploc`` runs the command line."""

from toploc.cli import main

if __name__ == "__main__":
    main()
