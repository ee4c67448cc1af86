"""Import path of the original Basic Module Util package, kept for old modules."""
