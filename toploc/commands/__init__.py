"""One module per ``toploc`` subcommand (or subcommand group); ``toploc.cli`` registers them."""
