"""``python -m toploc`` runs the command line."""

from toploc.cli import run

if __name__ == "__main__":
    run()
