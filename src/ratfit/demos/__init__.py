"""Built-in demonstrations on built-in data (the addendum's section 2).
"""

