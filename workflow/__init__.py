"""gridshell workflow: project files, stage runner with caching, command line, report."""
