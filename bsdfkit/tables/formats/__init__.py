"""tables/formats"""
