"""mlagents-like: a fast trainer server for Unity ML-Agents builds."""
__version__ = "0.1.0"
