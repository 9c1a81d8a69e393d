"""The GPS driver (services/gps): `python services/gps`, `python -m services.gps` or
`miro run gps` start it; __main__.py says how it works."""
