"""Dataset tools: ground truth from bursts (seed section 5.3)."""
