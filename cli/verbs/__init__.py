"""The verbs of the command line, one module per stage of the work."""
