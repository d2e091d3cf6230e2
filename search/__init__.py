"""Architecture search over zoo variants: axes, trials, runners, reports."""
