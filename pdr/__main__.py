from pdr.cli.main import entry_point

entry_point()
