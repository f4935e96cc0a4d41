"""Every error the runtime raises on purpose, as one tree.

::

    EdgeError
    ├── InputError            bad data from a file, a sensor stream or a flag: one line, exit 2
    │   ├── CliError          found by a command's own argument checks
    │   ├── ConfigError       the box configuration (TOML) or an override
    │   └── ...               each reader's own (KeypointInputError, CalibrationError, ...)
    ├── ModelIntegrityError   a shipped model that is missing, altered or of the wrong contract
    │   └── ManifestError     manifest.json itself
    └── LinkError             a bus, serial line or arm link that cannot be opened or used

Feature modules subclass these for their own messages; the command layer
(``edge_runtime.cli.run_command``) turns ``InputError``, ``ModelIntegrityError`` and a
``LinkError`` that stops a command (a bus or line that cannot be opened) into one line
and exit status 2. The loops themselves never raise ``LinkError`` on a fault they can
ride out: they count it and report it in their status instead.

The input kinds subclass ``ValueError`` (and ``LinkError`` subclasses ``RuntimeError``)
so that code written against the standard types keeps working.
"""
from __future__ import annotations


class EdgeError(Exception):
    """Base of every error the runtime raises on purpose; anything else is a bug."""


class InputError(EdgeError, ValueError):
    """Bad input: a file, line, field, flag or sensor message the runtime refuses."""


class CliError(InputError):
    """Bad input found by a command itself; the message is the whole story."""


class ConfigError(InputError):
    """A box configuration value, section or file that is not valid."""


class ModelIntegrityError(EdgeError, ValueError):
    """A model file that is missing, altered, or not what its manifest entry says."""


class ManifestError(ModelIntegrityError):
    """manifest.json is missing, unreadable or malformed."""


class LinkError(EdgeError, RuntimeError):
    """A bus, serial line or robot link that cannot be opened or does not carry traffic."""


BAD_INPUT: tuple[type[BaseException], ...] = (InputError, ModelIntegrityError)
"""What every command reports as one line and exit status 2."""
