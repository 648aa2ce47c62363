"""Pictures and the HTML report (matplotlib; imported only when a picture is drawn).
"""

