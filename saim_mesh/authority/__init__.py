"""What commanders send down the chain and confirmations up: commands to an EA, directives, plan versions."""
