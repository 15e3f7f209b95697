"""ftc_hw/scene"""
