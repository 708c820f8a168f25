"""The ``stmpl`` command line: the parser, the shared options and the commands."""
