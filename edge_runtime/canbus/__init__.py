"""CAN plumbing shared by the wearable and the robot link: opening a python-can bus, AUTOSAR E2E, DBC loading. Imports no feature."""
