"""gridshell workflow: project files, stage runner with caching, command line, report."""

import logging

# the library logs to its module loggers; an application (the CLI: --verbose) adds handlers
logging.getLogger(__name__).addHandler(logging.NullHandler())

