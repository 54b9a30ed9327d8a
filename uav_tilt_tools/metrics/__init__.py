"""The mission's and its tasks' metrics, shared by the report, the runner and the campaign."""
