"""The robot: base driver, panorama capture, and a simulated robot in a rendered world."""
