"""The results store: its protocol, schema, migrations and the SQLite backend."""
