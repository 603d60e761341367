"""Data for identification: recorded runs and plain tables to IdentificationData, preprocessing."""
