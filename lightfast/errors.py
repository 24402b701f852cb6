"""The exception root of lightfast. Each package area derives its own errors from :class:`LightfastError`."""


class LightfastError(Exception):
    """Base class of every error lightfast raises on purpose. CLIs map it to a one-line message and exit code 1."""
