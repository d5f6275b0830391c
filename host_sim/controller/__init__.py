"""What a controller reads and writes each cycle (Sense, Actuate), the firmware in the loop, and its rule base."""
