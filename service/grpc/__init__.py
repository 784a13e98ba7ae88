"""The gRPC front end: the Localizer servicer, StreamDetect's lanes and the message conversions."""
