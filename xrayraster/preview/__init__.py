"""``xrayraster preview``: radiographs of a scene or scan file in a web page, live as its settings
change (docs/preview.md). Needs the preview extra: ``pip install "xrayraster[preview]"``."""
