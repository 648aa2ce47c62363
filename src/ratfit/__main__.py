"""``python -m ratfit``: the command line."""

from ratfit.cli import main

if __name__ == "__main__":  # pragma: no cover
    main(prog_name="ratfit")
