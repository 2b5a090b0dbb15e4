"""Pictures of each stage (matplotlib, Agg backend, PNG). One module per stage."""
