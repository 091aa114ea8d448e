"""Contact theory: free-motion groups, classes, Table V enumeration and analysis.

numpy and scipy only; never imports cadquery.
"""
