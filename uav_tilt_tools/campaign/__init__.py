"""Campaigns: many randomised missions in-process, locally or on Ray, kept as they finish."""
