"""`miro new`: scaffold a service in one of the manual's design patterns (templates/service/)."""
