"""For people: figures (matplotlib) and a self-contained HTML audit page of a charging run."""
