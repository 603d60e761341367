"""Model structures to identify: physical pantograph, oscillators, black box, collector head."""
