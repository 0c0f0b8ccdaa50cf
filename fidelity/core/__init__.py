"""The shared core: errors, the version, shipped resources, file I/O, schemas and settings."""
