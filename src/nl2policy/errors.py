"""The one kind of error a user can fix by changing what they asked for or where it points
(a missing corpus folder, an unreadable file): the CLI prints its message as one line and exits
2, the API answers 4xx. Nothing heavy is imported here."""


class UserError(Exception):
    """An error whose message says what was wrong and what to do."""
