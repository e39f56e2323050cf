"""The package's version, in a module of its own so that any module can name it without
importing the package (whose __init__ imports the codec)."""

__version__ = "0.1.0"
