"""The laser scanner driver (services/laser): `python services/laser`, `python -m services.laser`
or `miro run laser` start it; __main__.py says how it works."""
