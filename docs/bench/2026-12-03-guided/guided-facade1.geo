scene facade1, database guided-facade1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 6 | 4803 | 93.4 % | 98.4 % | 100.0 % | 0.17 | 4803 | 86.7 % | 97.1 % | 99.9 % |
| view0.png view2.png | 6 | 4268 | 92.3 % | 98.7 % | 100.0 % | 0.19 | 4268 | 86.5 % | 97.3 % | 99.9 % |
| view0.png view3.png | 6 | 3833 | 91.3 % | 97.9 % | 100.0 % | 0.22 | 3833 | 83.5 % | 96.5 % | 99.7 % |
| view0.png view4.png | 2 | 682 | 44.4 % | 47.8 % | 52.1 % | 3.16 | 682 | 39.6 % | 43.5 % | 44.0 % |
| view1.png view2.png | 6 | 4598 | 93.1 % | 98.3 % | 100.0 % | 0.20 | 4598 | 86.9 % | 97.3 % | 99.9 % |
| view1.png view3.png | 6 | 4314 | 92.0 % | 98.2 % | 100.0 % | 0.22 | 4314 | 85.8 % | 97.0 % | 99.8 % |
| view1.png view4.png | 6 | 3524 | 91.3 % | 97.7 % | 99.9 % | 0.21 | 3524 | 83.4 % | 95.4 % | 99.6 % |
| view2.png view3.png | 6 | 4666 | 92.2 % | 98.2 % | 100.0 % | 0.21 | 4666 | 86.2 % | 96.9 % | 99.8 % |
| view2.png view4.png | 6 | 3980 | 92.6 % | 98.2 % | 100.0 % | 0.19 | 3980 | 85.8 % | 96.6 % | 99.9 % |
| view3.png view4.png | 6 | 4475 | 92.9 % | 98.7 % | 100.0 % | 0.18 | 4475 | 86.9 % | 97.3 % | 100.0 % |
| all pairs |  | 39143 | 91.6 % | 97.4 % | 99.1 % | 0.20 | 39143 | 85.0 % | 96.0 % | 98.9 % |

model: 5/5 images registered, 6441 points
relative rotation error (every pair of images, no alignment): mean 0.010° max 0.017°
after a similarity alignment of the camera centres: centre error mean 0.0017 max 0.0026 (scene units), rotation error mean 0.041° max 0.048°
