"""The ``sofac`` command line: argument parsing (main), the commands, report formats, inspect."""
