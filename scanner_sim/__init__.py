"""scanner_sim: the survey-mission simulator around the MULS lidar model."""
