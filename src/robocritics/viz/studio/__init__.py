"""The RoboCritics studio: a local web app to write, check and replay robot programs (issue 12)."""
