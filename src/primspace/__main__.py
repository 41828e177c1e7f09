"""``python -m primspace`` runs the command-line interface."""

from primspace.cli import main

if __name__ == "__main__":
    main()
