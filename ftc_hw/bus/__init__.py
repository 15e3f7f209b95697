"""ftc_hw/bus"""
