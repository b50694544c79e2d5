module tactile.example/proto

go 1.19

require (
	github.com/google/flatbuffers v2.0.8+incompatible
	github.com/gorilla/websocket v1.5.3
)
