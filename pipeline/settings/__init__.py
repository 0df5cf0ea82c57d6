"""Settings read from files, shared by every floor: the checked TOML fields (the protocol file and the hardware file
use them) and the hardware settings."""
