"""The one kind of error a tool raises for bad user input: cli.py prints it as one line, exit 2."""


class InputError(LookupError):
    """Bad input from the command line (a path, a value, a name); the text names it and the value."""
