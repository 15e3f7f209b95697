"""sim_devices/world"""
