"""ENI model and parser (pure: strings and bytes in, values out)."""
