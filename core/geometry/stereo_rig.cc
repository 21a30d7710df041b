// PLACEHOLDER: being implemented this session.
