//! One module per `tribo` subcommand: its clap arguments and the function that runs it.
