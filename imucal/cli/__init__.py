"""The command line: argument parsing, one option set per concern, exit statuses."""
