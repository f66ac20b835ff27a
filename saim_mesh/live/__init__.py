"""Live mesh without a centre: ordering facts from many sources by event time."""
