"""One module per kind, each registering a name that aveas-format already has."""
