"""The ``aoc`` command: thin typer modules that parse flags, call the library and print."""
