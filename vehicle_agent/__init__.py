"""The on-vehicle agent: CAN, car state per make, controllers, actuation, plan client, spool.

Runs on a Raspberry Pi class computer with its own settings; it never imports `app`.
"""
