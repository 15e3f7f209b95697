"""ftc_hw/model"""
