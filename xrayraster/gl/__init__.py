"""OpenGL: the headless context, ray setup, exact crossings, path lengths and label volumes."""
