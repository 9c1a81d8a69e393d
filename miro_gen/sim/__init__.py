"""Simulated devices, so that drivers can be run and tested without hardware (`miro sim`)."""
