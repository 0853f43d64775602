"""What tests share that is not a fixture: scenes built in code, the wire's clients, the browser."""
