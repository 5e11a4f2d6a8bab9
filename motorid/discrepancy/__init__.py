"""When model and recordings differ: locate, name the missing physics, model it."""
