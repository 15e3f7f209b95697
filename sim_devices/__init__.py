"""sim_devices"""
