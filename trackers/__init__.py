"""Pure tracking computation: models, filters, association, scoring, the tracking step.

Only numpy, scipy and the standard library are used here; times come in as arguments.
"""
