"""One module per ``selfalign`` subcommand."""
