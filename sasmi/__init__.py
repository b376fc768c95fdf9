"""sasmi: artificial synthetic-aperture-sonar images with full control over the scene."""
__version__ = "0.1.0"
