"""The EAs in one process over a scenario's events (the reference every mesh run is compared with), scored and drawn."""
