"""Processes that relay events between miro-gen's channels and other middleware's."""
