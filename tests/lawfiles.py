"""The suite's law files of a user's own that end or fail their flight: their common hovering part.

In:  nothing
Out: :data:`HOVERING`, the source of a class ``_Hovering`` (the law contract of docs/usage.md, "Plug in your own
     law": it holds the hover thrust), for a test's law file to subclass with the ``update`` that ends its worker
     or fails its flight
"""

HOVERING = """

class _Hovering:  # holds the hover thrust: a subclass's update ends or fails the flight
    def __init__(self, nominal, gains, rate_hz):
        self.m, self.g = nominal.mass, nominal.gravity
        self.desired = (0.0, 0.0)

    def advance(self, saturated, hold=False):
        pass

    def reset(self):
        pass
"""
