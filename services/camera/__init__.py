"""The camera service (services/camera): `python services/camera`, `python -m services.camera`
or `miro run camera` start it; __main__.py says how it works."""
