"""Studies that reproduce the seed papers and analyse real data with casship's public API."""
