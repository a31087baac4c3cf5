"""The vehicle contract: what server and car both rely on, so the two never drift apart.

The wire models (pings, status, vehicle config, plan document, error shape), the units, the
corridor geometry, the IDM and the readers of the recorded data. It depends on pydantic and
numpy only and imports nothing else of smoothfleet: everything else may import it.
"""
