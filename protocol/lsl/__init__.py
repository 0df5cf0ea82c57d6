"""The session on the Lab Streaming Layer: its outlets (the force streams, the trial markers) and the external
streams it records (docs/lsl.md).  Below the session runner, above the storage it writes through."""
