"""Pictures: figures of scenes and predictions, the rendered body under contact, the
speed-vs-accuracy chart, and mesh export for other viewers.
"""
