"""Results: fit results (data, persistence, text and JSON summaries) and their figures and residual views."""
