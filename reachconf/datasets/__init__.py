"""Readers of public data sets used by the use cases (BIWI pedestrians, OpenFAST output)."""
