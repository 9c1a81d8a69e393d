"""Event logs on MCAP: Miro's LogNotify (`miro log record`) and LogPlayer (`miro log play`),
the file tools (`miro log info`, `miro log echo`) and the live ones (`miro echo`, `miro hz`).

A log holds, for each `domain/type` topic, the events' CDR payloads exactly as they travelled,
with the type's data schema (OMG IDL, so Foxglove and the `mcap` tools open the files). See
docs/LOGS.md for the file layout and what a replay reproduces.
"""
