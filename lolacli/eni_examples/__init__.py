"""eni_examples."""
