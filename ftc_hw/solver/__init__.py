"""ftc_hw/solver"""
