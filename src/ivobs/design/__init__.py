"""Offline design: observer gains from LMIs, similarity and Sylvester transformations, parity
matrices. Nothing here loops over time; every function checks what it computed and raises
:class:`ivobs.DesignError` naming the condition that could not be met."""
