"""The `landscape` command-line tool (console script); see app.py."""
