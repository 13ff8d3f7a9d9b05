"""The gateway's error for a CRCL command it cannot carry out."""


class CrclError(Exception):
    """A command that cannot be carried out; the text becomes its StateDescription."""
