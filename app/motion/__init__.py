"""I-24 MOTION analytics: import, Edie fields, the bulk-fuel figure (docs/analytics.md)."""
