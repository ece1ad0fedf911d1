"""REST API: a thin FastAPI layer over the service module."""
