"""trace/oracles"""
