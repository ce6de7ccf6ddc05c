"""The bench application: command line, configuration, storage, reports."""
